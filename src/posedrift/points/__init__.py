"""points"""

__all__: list[str] = []
