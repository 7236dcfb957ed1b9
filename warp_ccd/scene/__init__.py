"""warp_ccd.scene."""
