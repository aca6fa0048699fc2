"""Surface room: waterlines at levels -> height map; seed methods; statistics. Pure."""
