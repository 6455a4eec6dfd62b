"""Importing this module registers every built-in filter (one import per filter module)."""
