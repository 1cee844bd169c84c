"""Geometry the bakes need without Blender: paper-scene height fields, UV layout checks."""
