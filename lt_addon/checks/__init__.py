"""Reproductions of the papers' own numbers with this package's core (`relight validate`)."""
