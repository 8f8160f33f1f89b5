"""Subcommands of the `gsgeo` command line, one module each."""
