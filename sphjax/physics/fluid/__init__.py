"""Fluids: equations of state, density, viscosity, density diffusion, momentum."""
