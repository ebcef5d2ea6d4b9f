"""The station and the controller in two processes: LCM messages (`lcm_messages`), the two
halves of the link (`interface`), the runs over it (`remote`) and the check that both sides
run the same scenario (`scenario_identity`)."""
