"""Rigid bodies: particles that move as one body, coupled to a fluid both ways."""
