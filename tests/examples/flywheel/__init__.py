"""An example model folder (README.md here): the walk-through of docs/models.md, "Adding a model"."""
