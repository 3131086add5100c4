"""LTAA allocation service."""
