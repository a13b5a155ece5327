"""Mechanics: link frames, bodies, loads and constraint rows built from a Document; the equations of motion."""
