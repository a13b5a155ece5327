"""The model language: YAML with positions, the schema, the whitelist expression parser, the loaded Document."""
