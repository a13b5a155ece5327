"""Motion: forward and inverse dynamics, events, output quantities, reactions and integrator studies."""
