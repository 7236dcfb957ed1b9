"""warp_ccd.geometry."""
