"""Fusion service: joins speech, vision and gesture on source time into grounded commands."""
