"""Vision room: frame -> binary -> sub-pixel waterlines in mm. Pure, integer-first."""
