"""warp_ccd.stages."""
