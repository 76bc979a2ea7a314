"""The physics models, one folder each (code and README.md, the model card); the registry of
FMU model names is catalog.py. A model imports the runtime and its own folder only."""
