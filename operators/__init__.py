"""bpy layer: operators, properties, panel, node trees and the CLI."""
