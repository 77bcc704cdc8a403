"""Vehicle model registry: name -> Model (see logscan.models.base for the interface)."""
