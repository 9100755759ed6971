"""Registers every command on the app (each lives in its own module)."""
