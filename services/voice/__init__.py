"""The robot's voice: fusion's questions and refusals spoken aloud (docs/voice.md)."""
