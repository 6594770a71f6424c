"""The steering model: data on a time grid, the Nomoto structure, its effects, the integrator, the simulator."""
