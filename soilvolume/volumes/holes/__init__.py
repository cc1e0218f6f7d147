"""Hole filling: interpolants and their error, a survey's own holes, the outline's, the unseen ones."""
