"""Vision service: objects with label, colour, box, score and stable ids, plus image quality, from frames."""
