"""Synthetic ground truth: a clothed, textured person on the body model, rendered as a mesh."""
