"""Gymnasium environment faces of the sorting line (the evolving line so far; the package
reorganisation moves the others here)."""
