"""Bench profiles shipped with the package (YAML data; paper.yaml is the default)."""
