"""The extending page's package (advanced/extending.md): a custom component and its config."""
