"""The command line: Typer commands (thin: parse, call one workflow, emit) and settings."""

from credcli.cli.app import app, entry, main

__all__ = ["app", "entry", "main"]
