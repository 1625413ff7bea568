"""Gesture service: MediaPipe hand and body landmarks -> point / wave / open palm / fist / thumbs-up, with a pointing
ray from the finger or the arm."""
