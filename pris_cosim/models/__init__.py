"""The thesis's built-in models, their test configurations and the grouped responses of those configurations."""
