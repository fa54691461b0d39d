"""The exact engine: the stick/slip switch model of Leine et al. (1998), event by event."""
