"""The parser of every `jaxchain` command and the error of a bad option: standard
library only, so that the commands that need no JAX (`jaxchain server`) start at
once."""

import argparse


class UsageError(Exception):
    """A bad option or value, found by a command's own checks: reported in one line,
    exit status 2, as the library's `ValidationError`."""


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr and exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")
