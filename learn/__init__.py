"""learn package."""
