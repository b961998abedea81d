"""Exploration data on disk: ``zsrm collect`` writes it, ``zsrm label`` captions it.

>>> from zsrm.data import CollectConfig, ExplorationData
>>> from zsrm.data.collect import collect
"""
from zsrm.data.collect import CollectConfig
from zsrm.data.dataset import ExplorationData

__all__ = ["CollectConfig", "ExplorationData"]
