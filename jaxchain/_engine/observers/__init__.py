"""Observers: what a run keeps of its trajectory, reduced chunk by chunk."""
