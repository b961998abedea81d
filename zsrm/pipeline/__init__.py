"""The pipeline's stages as commands, and the report: the top of the library.

Each command of ``zsrm`` is a dataclass here whose fields are its options (defaults written
once, help from the field comments) and whose ``run()`` does the stage; the CLI only turns
the command line into one of them (:mod:`zsrm.cli`).

* :mod:`zsrm.pipeline.build`: stages that make data and models (pretrain-vlm, collect,
  label, reward-data, finetune);
* :mod:`zsrm.pipeline.measure`: stages that measure (render, scripted-eval, eval-vlm,
  reward, reward-curve, eval-grounding, eval-reward);
* :mod:`zsrm.pipeline.goals`: goal sentences (parse-goal, eval-goals);
* :mod:`zsrm.pipeline.demo`: the offline main job's report (``zsrm demo``).
* :mod:`zsrm.pipeline.reproduce` and :mod:`zsrm.pipeline.report`: ``zsrm reproduce`` and its report;
* :mod:`zsrm.pipeline.results_page`: ``results/README.md`` and README.md's headline table, read from
  the result files (``zsrm results-page``).
"""
from __future__ import annotations

import dataclasses


def narrow(options, cls):
    """The ``cls`` part of command options that extend the dataclass ``cls`` (e.g. the config a
    stage stores in its manifest, without the command's own ``--out`` or ``--quiet``)."""
    return cls(**{f.name: getattr(options, f.name) for f in dataclasses.fields(cls) if f.init})
