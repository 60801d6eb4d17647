"""Rerun: entity paths, the default blueprint, archetype conversion and the logger thread."""
