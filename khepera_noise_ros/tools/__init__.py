"""Maintenance tools: ``param_docs`` and ``effect_docs`` write docs/parameters.md and
docs/effects.md (``generated``: write a page, or check it is current)."""
