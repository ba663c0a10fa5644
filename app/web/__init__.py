"""The HTTP side: the FastAPI app, its pages, request context, security, transport and `foil serve`."""
