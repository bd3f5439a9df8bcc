"""Maintenance tools: ``param_docs`` writes docs/parameters.md from the nodes' descriptors."""
