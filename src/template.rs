//! IRL template parsing and parameter substitution (being written).
