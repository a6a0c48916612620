"""Model wrappers (text and vision encoders) loaded from local files only."""
