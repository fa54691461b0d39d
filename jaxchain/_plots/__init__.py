"""Matplotlib figures of the paper's scenes, one file per figure.

Each function draws a new pyplot figure and returns it, and leaves the backend to
the user: inline in Jupyter, a window with `plt.show()`, or a file with
`fig.savefig` on any backend (the command line chooses Agg for itself)."""
