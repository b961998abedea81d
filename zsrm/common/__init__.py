"""What every layer shares, below them all: files, saved models and checkpoints.

* :mod:`zsrm.common.files`: JSON in and out, atomic writes, :class:`~zsrm.common.files.ZsrmFileError`
  (one clear line for a bad file or an unwritable path).
* :mod:`zsrm.common.registry`: the one folder format of a saved model (``config.json`` naming its
  kind, safetensors weights), the registry of kinds and their loaders, configs checked against
  dataclasses.
* :mod:`zsrm.common.checkpoints`: optimiser state and training checkpoints a killed run resumes
  from (AdamW, warmup-cosine schedule).

It imports nothing else of zsrm.
"""
