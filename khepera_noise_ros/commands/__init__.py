"""Subcommands of ``khepera-noise``; each module is found and added automatically."""
