//! Training (schedule, clipping, loop) of dgstereo models.
