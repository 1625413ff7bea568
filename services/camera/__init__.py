"""Camera service: frames from a webcam, a video file, an image file or a folder of images."""
