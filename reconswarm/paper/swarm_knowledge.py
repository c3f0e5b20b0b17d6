"""Every agent's obstacle knowledge at once, for the in-process engine (reconswarm/paper/knowledge.py states the
rule). Pure, no zenoh.

Knowledge of obstacle l is a bitset over l's contour samples (one bit a sample, l's block of bytes). Two
storages give the same bits, hulls and `version` steps behind the one interface `SwarmKnowledge`:

- `DenseKnowledge` (reconswarm/paper/dense_knowledge.py): one (N, B) table, a bit per contour sample for
  every agent. Fewest numpy calls a tick: the choice while the table is small.
- `SparseKnowledge` (reconswarm/paper/sparse_knowledge.py): a block of l only for agents that know something
  of l. Memory grows with what the agents know: the choice for large swarms.

`SwarmKnowledge(samples, start, count, n_agents)` (reconswarm/paper/knowledge_bits.py: the interface) makes
the dense one when N x B bytes are at most `DENSE_MAX_BYTES` (64 MiB), the sparse one beyond;
`dense=True/False` chooses explicitly.
"""

from reconswarm.paper.dense_knowledge import DenseKnowledge
from reconswarm.paper.knowledge_bits import DENSE_MAX_BYTES, SwarmKnowledge
from reconswarm.paper.sparse_knowledge import SparseKnowledge

__all__ = ["DENSE_MAX_BYTES", "DenseKnowledge", "SparseKnowledge", "SwarmKnowledge"]
