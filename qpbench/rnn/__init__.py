"""The paper's recurrent neural network (eq. 15) as a general QP solver.

:mod:`qpbench.rnn.network` holds the network; the backends ``rnn``, ``rnn-tuned`` and
``rnn-converged`` (:mod:`qpbench.backends.rnn`) wrap it.
"""
