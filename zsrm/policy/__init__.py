"""One policy for many sentences: multi-task behaviour cloning (paper 2.3 and 3.3, Table 2).

* :mod:`~zsrm.policy.rollouts`: rollouts of the 18 zsrm-trained task policies, in shards with
  their goal text (``zsrm multitask-rollouts``); blue never appears in them;
* :mod:`~zsrm.policy.models`: the language-conditioned, primitive-code and unconditioned
  policies, saved as safetensors + JSON;
* :mod:`~zsrm.policy.training`: behaviour cloning of the three (``zsrm distill``).
"""
