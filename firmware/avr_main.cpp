/*
 * avr_main.cpp - main() for the plain avr-libc build (the Arduino core
 * provides its own when the sketch is built in the IDE).
 */
void setup();
void loop();

int main()
{
	setup();
	for (;;)
		loop();
}
