"""Speech service: audio -> voice activity -> offline recognition -> timed Transcripts."""
