"""The command line: Typer commands (thin: options -> one typed request -> one workflow ->
emit), their options, settings, output and the exit-code edge."""

from credcli.cli.app import app
from credcli.cli.edge import entry, main

__all__ = ["app", "entry", "main"]
