"""Control: the feedback-linearising controller, the ground-effect models, the land detector."""
