"""Video off the GUI thread: latest-frame mailboxes, JPEG decoding and image correction.

Qt-free (numpy and OpenCV), so it is tested without a display; ocu.qt.link wraps the
decoded pixels into QImages and ocu.widgets.video_view paints them.
"""
