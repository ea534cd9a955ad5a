"""The appliance's own web page: live state, results with their plots, history, set-up.

``WebServer`` (``service.publish.web.server``) runs an aiohttp server in its own
thread inside the daemon. Pages are rendered on the server (Jinja2); a little
plain JavaScript draws the live swing from server-sent events. Nothing is
fetched from outside the appliance. Read-only pages are open on the bound
interface; actions need the token (``service.publish.web.auth``). ``views`` holds
the route table and the middlewares; the pages are one module per page family,
each a small class on the context every page shares (``pages``).
"""
