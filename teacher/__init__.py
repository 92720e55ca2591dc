"""The ConAg teacher (paper §5.1): reinforces students' construction decisions.

Pure core (no zenoh): `core` (compare a student's Decision with the engineered network
of Fig. 8, answer +1 / -1 for the arm and the motor output) and `trials` (learning
trials in one process for the Fig. 9 experiment). Shell: `process` (`conag teacher`).
The student's side is `agent_runtime.learning` (the delta rule), `agent_runtime.qlearning`
and `agent_runtime.student_link`.
"""
