"""Subcommands beyond run/build: each module defines register(subparsers)."""
