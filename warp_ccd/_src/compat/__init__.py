"""Bridges to other libraries' simulations: warp_ccd's results written where their solvers read them
(:mod:`~warp_ccd._src.compat.newton`: mesh-mesh contacts for newton's rigid-body solvers). Each imports its
library inside its own module: importing warp_ccd never imports them."""
