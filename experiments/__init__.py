"""trackmj scenario files W1-W5 (TOML) and scripted studies."""
