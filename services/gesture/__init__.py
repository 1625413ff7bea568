"""Gesture service: MediaPipe hand landmarks -> point / wave / open palm / fist / thumbs-up, with a pointing ray."""
