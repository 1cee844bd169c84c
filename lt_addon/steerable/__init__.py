"""Steerable illumination textures (Ashikhmin & Shirley 2002): basis lights and textures."""
