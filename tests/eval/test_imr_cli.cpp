// `d2gs imr` end to end: added once PLY I/O has landed.
