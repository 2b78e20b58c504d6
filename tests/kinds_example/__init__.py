"""Measurement kinds written the way a user adds one: one folder each, loaded with
``--plugin FOLDER`` (tests/integration/test_example_kind.py)."""
