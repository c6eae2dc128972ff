"""The map: vector generation from the side sonars, the map module's vector store and the GET_MAP
requester."""
