"""credcli's version, written once: the package metadata (``pyproject.toml`` reads it
from here), ``credcli --version`` and every JSON document's ``version``."""

__version__ = "0.1.0"
