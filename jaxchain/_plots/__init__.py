"""Matplotlib figures of the paper's scenes, one file per figure."""
