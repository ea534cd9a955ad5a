"""Publishers: what the appliance tells the plant (Modbus registers, MQTT, the web page) and the payload they share."""
