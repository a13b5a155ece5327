"""Numeric callables from the symbolic model (common-subexpression elimination, then numpy)."""
