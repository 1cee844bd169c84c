"""Directions on the sphere: hemisphere maps, direction sets with solid angles, SH / Haar bases."""
