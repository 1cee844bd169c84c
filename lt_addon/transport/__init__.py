"""Sampled light transport: textures, eigentransport, CPCA and its cost theory, sidecars."""
