"""Every random stream of spikectl, with its number and who draws from it.

A run has two seeds: ``EnvConfig.context_seed`` (which networks) and ``TrainConfig.seed``
(everything the training draws). Each fans out into independent streams keyed by a number,
``numpy.random.SeedSequence([seed, STREAM, ...])``. The numbers are part of every committed
result: changing one changes what a seed gives, so none may change or be reused.

=================================  =======  ==============================================
stream                             entropy  consumer
=================================  =======  ==============================================
context seed, main                 seed     training and test sets (``make_splits``)
``VALIDATION_STREAM``              [s, 1]   the validation set (``make_validation_set``)
training seed, main                s        the loop's generator: context choice, then the
                                            learner's draws (exploration, replay, minibatch
                                            order), one order for a run and its resume
``AUX_HEAD_STREAM``                [s, 1]   the auxiliary next-voltage head's initialisation
``CONNECTIVITY_HEAD_STREAM``       [s, 2]   the guided learner's connectivity head
``COLLECT_STREAM``                 [s,2,e]  the collecting environments' own draws (noise,
                                            stochastic release) after ``e`` episodes
``EVAL_STREAM``                    [s, 3]   the evaluation environments' own draws (the
                                            same at every evaluation)
=================================  =======  ==============================================

A controller has a seed of its own (``spikectl.load_controller(..., seed=s)``; where a
vector environment plays copies of one, copy i gets ``s + i``):

=================================  =======  ==============================================
``RandomLegal(seed)``              s        its uniform legal actions
``AmortisedController(seed=s)``    s        its ``"thompson"`` rule's draws
``IdentifyAndPlan(seed=s)``        [s, e]   the networks episode ``e`` draws from the
                                            estimate (QMDP's, the planned hypotheses')
=================================  =======  ==============================================

Under one seed a number names one stream: ``AUX_HEAD_STREAM`` and ``VALIDATION_STREAM``
are both 1 but under different seeds, and ``[s, 2]`` (a Torch seed, 32 bits) and
``[s, 2, e]`` (an environment seed, 63 bits) are different entropy, so no two consumers
share draws.
"""

from __future__ import annotations

import numpy as np

VALIDATION_STREAM = 1
"""Under ``context_seed``: the validation set, drawn from ``default_rng([seed, 1])``."""
AUX_HEAD_STREAM = 1
"""Under the training seed: the auxiliary next-voltage head's Torch initialisation."""
CONNECTIVITY_HEAD_STREAM = 2
"""Under the training seed: the connectivity head's Torch initialisation (guided learner)."""
COLLECT_STREAM = 2
"""Under the training seed, with the episode count: the collecting environment's draws."""
EVAL_STREAM = 3
"""Under the training seed: the evaluation environments' own draws."""


def torch_seed(seed: int, stream: int) -> int:
    """A Torch seed (32 bits) for stream ``stream`` of ``seed``."""
    return int(np.random.SeedSequence([seed, stream]).generate_state(1)[0])


def environment_seed(seed: int, stream: int, *more: int) -> int:
    """An environment seed (63 bits) for stream ``stream`` of ``seed`` (and ``more``)."""
    entropy = [seed, stream, *more]
    return int(np.random.SeedSequence(entropy).generate_state(1, np.uint64)[0] >> 1)
