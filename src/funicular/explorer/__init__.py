"""``funicular serve``: an interactive explorer in the browser. The domain (state -> problem -> solve ->
JSON) is :mod:`funicular.explorer._state`; the web application (Starlette) is
:mod:`funicular.explorer._app`, loaded only by the command."""
