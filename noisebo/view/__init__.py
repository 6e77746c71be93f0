"""Campaign views: frames (pure), the Rerun recording and the report figures."""
