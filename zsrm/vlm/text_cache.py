"""The one text-embedding cache: every frozen text tower in zsrm (the scene VLM's sentence
encoder, the student's and the adapted VLM's reference, Grad-CAM's phrases, the rewards' goal
texts) runs once per distinct text."""
from __future__ import annotations

from typing import Callable, Sequence

import torch


class TextEmbeddingCache:
    """Text embeddings computed once per distinct text and reused.

    ``encode`` maps a list of texts to a ``(M, D)`` tensor; texts missing from the cache are
    encoded together in one call. With ``enabled=False`` every call encodes (the simple way,
    kept for benchmarks). The cache assumes a frozen text tower: call :meth:`clear` after
    changing its weights.

    >>> import torch
    >>> calls = []
    >>> cache = TextEmbeddingCache(lambda texts: calls.append(texts) or torch.ones(len(texts), 4))
    >>> cache(["a red block"]).shape, cache(["a red block", "a blue block"]).shape
    (torch.Size([1, 4]), torch.Size([2, 4]))
    >>> calls  # the second call encoded only the new text
    [['a red block'], ['a blue block']]
    """

    def __init__(self, encode: Callable[[list[str]], torch.Tensor], enabled: bool = True):
        self.encode = encode
        self.enabled = enabled
        self._store: dict[str, torch.Tensor] = {}
        self.hits = 0
        self.misses = 0

    def __call__(self, texts: Sequence[str]) -> torch.Tensor:
        texts = [texts] if isinstance(texts, str) else list(texts)
        if not self.enabled:
            self.misses += len(texts)
            with torch.no_grad():
                return self.encode(texts)
        missing = list(dict.fromkeys(t for t in texts if t not in self._store))
        self.hits += len(texts) - len(missing)
        self.misses += len(missing)
        if missing:
            with torch.no_grad():
                emb = self.encode(missing)
            for text, e in zip(missing, emb):
                self._store[text] = e
        return torch.stack([self._store[t] for t in texts])

    def __contains__(self, text: str) -> bool:
        return text in self._store

    def __len__(self) -> int:
        return len(self._store)

    def clear(self) -> None:
        self._store.clear()
