"""An example model folder (README.md here): the walk-through of the README's "Adding a model"."""
