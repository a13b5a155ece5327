"""Impact: impulse-momentum collisions, alone and inside simulations."""
