"""Figure specifications per chapter and their interactive and static rendering.
"""

__all__: list[str] = []
