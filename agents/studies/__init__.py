"""Studies behind the documentation's analyses (``python -m agents.studies.<name>``)."""
