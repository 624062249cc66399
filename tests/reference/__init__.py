"""Independent references (Mitsuba 3) for the radiosity solver tests."""
