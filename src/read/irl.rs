//! IRL reader (being written).
