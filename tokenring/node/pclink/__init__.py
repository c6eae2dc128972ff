"""main's end of the PC link, the seed's serial line: the server and its system verbs."""
