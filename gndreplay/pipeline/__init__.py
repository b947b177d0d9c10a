"""The navigation stack: model builder, planners, reactor, supervisor. Never imports io/ or report/."""
