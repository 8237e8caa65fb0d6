"""fabwire on an MQTT broker: the `fabwire serve --mqtt` bridge (state, availability, events, commands and Home
Assistant discovery per device) and `fabwire fleet`. Needs `fabwire[mqtt]`."""
