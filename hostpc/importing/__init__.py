"""Importers: turn what metrology software exports into zerocal datasets (pure functions)."""
