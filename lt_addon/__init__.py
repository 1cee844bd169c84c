"""Blender-free core of Relightable Textures: NumPy/SciPy only.

Never import bpy or mathutils here (a test enforces it). Arrays in, arrays out.
"""
