"""Example generators: run them as scripts, or import them from the repository root."""
