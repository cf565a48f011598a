"""Inverse design on top of jaxrod (issue 5)."""
