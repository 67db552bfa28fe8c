"""The modelgen version (one place; part of every generated file's preamble and cache key)."""
__version__ = "0.1.0"
