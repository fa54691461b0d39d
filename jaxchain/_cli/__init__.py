"""The `jaxchain` command line."""
