"""Core types: State, Params, Model, Case; kernels, space and neighbour search."""
