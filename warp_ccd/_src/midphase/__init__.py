"""Mid phase: candidate triangle pairs of the broad phase's object pairs: tree against tree (and whole
small objects triangle by triangle), and the all-pairs reference."""
