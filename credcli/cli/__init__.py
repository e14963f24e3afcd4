"""The command line: Typer commands (thin: options -> one typed request -> one workflow ->
emit), their options, settings, output and the exit-code edge. The Typer app is
``credcli.cli.app.app`` (the package does not re-export it: ``credcli.cli.app`` stays the
module)."""

from credcli.cli.edge import entry, main

__all__ = ["entry", "main"]
