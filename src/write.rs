//! Atomic writes and the blackboard write-back splice (being written).
