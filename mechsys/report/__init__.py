"""Rendering: text, Markdown, LaTeX, JSON and tables of models and results, and the files they are written to."""
