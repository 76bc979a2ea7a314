"""The DC servo motor (stephenson_press_servo_drive.txt): armature lag, speed loop, limits. See README.md."""
