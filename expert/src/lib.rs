//! The model-based distance formation controller (the expert) and demonstration collection.
