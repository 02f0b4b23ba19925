"""Robot descriptions (YAML, SI units) loaded into immutable model objects."""
