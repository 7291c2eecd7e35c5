"""Integration: the kick-drift-kick step, the ``lax.scan`` driver and the diffrax solver."""
