"""Subcommands of the `hexa` CLI. Each module defines `register(subparsers)`; cli.py discovers them."""
