"""Files in and out: reading a user's file (``inputs``) and writing atomically (``outputs``)."""
