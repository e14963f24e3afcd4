from credcli.cli import entry

entry()
