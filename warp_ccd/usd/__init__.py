"""warp_ccd.usd."""
