"""Deterministic sample-scene builders (bpy)."""
