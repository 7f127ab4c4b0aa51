"""The thesis's experiments (chapter 4): definitions, campaigns, reports."""
