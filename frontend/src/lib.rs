//! Parallax front end: the coordinator.
