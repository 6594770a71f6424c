"""Subcommands of ship-ident, one module each."""
