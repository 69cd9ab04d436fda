"""Bundled scene files (TOML), found with ``importlib.resources``."""
