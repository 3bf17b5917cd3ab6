"""The language front end: parse G-code text, interpret modal state into path segments."""
