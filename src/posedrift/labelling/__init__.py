"""labelling"""

__all__: list[str] = []
