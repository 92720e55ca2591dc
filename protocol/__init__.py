"""The bus protocol shared by every ConAg process: key expressions, message types, codec.

This is the only code the world server, the agents and the teacher share. It imports
no zenoh: key expressions are plain strings and messages are plain bytes.
"""

from protocol.codec import MAX_MESSAGE_BYTES, ProtocolError, decode, encode
from protocol.messages import (
    ACTIONS,
    BEHAVIOURS,
    CHANNELS,
    DISC_KINDS,
    MESSAGE_TYPES,
    PERTURB_OPS,
    SCHEMA_VERSION,
    AgentCommand,
    AgentState,
    Blueprint,
    CommandRejected,
    Decision,
    Hello,
    LockstepTimeout,
    Perturbation,
    Perturbed,
    PerturbResult,
    Reinforcement,
    RunControl,
    RunControlResult,
    SensorFrame,
    Welcome,
    WorldStatus,
    WorldView,
)

__all__ = [
    "ACTIONS",
    "BEHAVIOURS",
    "CHANNELS",
    "DISC_KINDS",
    "MAX_MESSAGE_BYTES",
    "MESSAGE_TYPES",
    "PERTURB_OPS",
    "SCHEMA_VERSION",
    "AgentCommand",
    "AgentState",
    "Blueprint",
    "CommandRejected",
    "Decision",
    "Hello",
    "LockstepTimeout",
    "PerturbResult",
    "Perturbation",
    "Perturbed",
    "ProtocolError",
    "Reinforcement",
    "RunControl",
    "RunControlResult",
    "SensorFrame",
    "Welcome",
    "WorldStatus",
    "WorldView",
    "decode",
    "encode",
]
