"""The Stephenson six-bar crank press (stephenson_press_servo_drive.txt). See README.md."""
