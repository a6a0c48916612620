"""One small least-recently-used table for the per-process caches (distance fields, ad-hoc goal
viewpoints): training resets revisit the same few goal sets thousands of times."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Any


class LRU:
    """`get(key, make)`: the cached value, else `make()` stored (the oldest entry dropped beyond `size`)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.table: OrderedDict[Any, Any] = OrderedDict()

    def get(self, key: Any, make: Callable[[], Any]) -> Any:
        hit = self.table.get(key)
        if hit is not None:
            self.table.move_to_end(key)
            return hit
        value = make()
        self.table[key] = value
        while len(self.table) > self.size:
            self.table.popitem(last=False)
        return value

    def clear(self) -> None:
        self.table.clear()

    def __len__(self) -> int:
        return len(self.table)
